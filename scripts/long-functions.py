#!/usr/bin/env python3
# Functions longer than LIMIT lines (default 80) in the C++ files named, longest first per file:
# a brace counter over the text with comments and strings blanked, not a parser (a function is
# a brace block whose head ends in a parameter list; lambdas count with their function).
# Usage: LIMIT=80 scripts/long-functions.py $(git ls-files 'src/*.cpp' 'src/*.h' 'apps/*.cpp')
import re, sys, os
LIMIT=int(os.environ.get('LIMIT','80'))
def strip(s):
    s=re.sub(r'//[^\n]*','',s)
    s=re.sub(r'/\*.*?\*/',lambda m: '\n'*m.group(0).count('\n'),s,flags=re.S)
    s=re.sub(r'R"(\w*)\((.*?)\)\1"',lambda m: '""'+'\n'*m.group(0).count('\n'),s,flags=re.S)
    s=re.sub(r'"(\\.|[^"\\\n])*"','""',s)
    s=re.sub(r"'(\\.|[^'\\\n])'","''",s)
    return s
for path in sys.argv[1:]:
    src=strip(open(path,errors='replace').read())
    lines=src.split('\n')
    stack=[]  # (kind, start_line, name)
    pending=''
    for ln,line in enumerate(lines,1):
        for ch_i,ch in enumerate(line):
            if ch=='{':
                head=(pending+line[:ch_i]).strip()
                pending=''
                kind='block'
                if re.search(r'\b(namespace|class|struct|union|enum)\b[^;()]*$',head) and not re.search(r'\)\s*(const)?\s*$',head):
                    kind='scope'
                elif re.search(r'\)\s*(const|override|noexcept|final|mutable|try|->\s*[\w:<>]+|\s)*$',head) and all(k!='func' for k,_,_ in stack):
                    if not re.search(r'\b(if|for|while|switch|catch)\s*\(',head.split(';')[-1]):
                        kind='func'
                name=re.findall(r'([\w:~]+)\s*\([^()]*\)?',head.split(';')[-1].split('}')[-1])
                stack.append((kind,ln,name[0] if name else head[-40:]))
            elif ch=='}':
                if stack:
                    kind,start,name=stack.pop()
                    if kind=='func' and ln-start+1>LIMIT:
                        print(f'{ln-start+1:5d} {path}:{start} {name}')
                pending=''
            elif ch==';':
                pending=''
        # keep the tail after the last brace/semicolon as the start of the next head
        tail=re.split(r'[{};]',line)[-1]
        pending=(pending+' '+tail) if not re.search(r'[{};]',line) else tail
